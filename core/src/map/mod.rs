// SPDX-License-Identifier: MIT
//! The map: where fused geometry lives, in one of two kinds behind one description
//! ([`VolumeDesc`], `shaders/wgsl/shared/map.wgsl`):
//!
//! - **dense** ([`DenseTsdfVolume`]): every voxel of a box, x fastest. Simple, and the
//!   reference the sparse map is tested against; a room does not fit in it.
//! - **sparse** ([`SparseMap`], voxel-block hashing after Nießner et al. 2013 and InfiniTAM):
//!   only blocks of 8³ voxels near measured surfaces are stored, in a bounded pool, and a hash
//!   table maps block coordinates to pool blocks. Its box is the addressable range of block keys
//!   (2048 x 2048 x 1023 blocks: 164 x 164 x 82 m at 1 cm voxels) centred on the first camera,
//!   so the world grows wherever the camera looks.
//!
//! Every kernel that reads a map reads both kinds (`map_lookup.wgsl`); integration differs:
//! the dense box is swept column by column in the frustum (`tsdf_integrate`), the sparse map
//! runs, per frame, `block_alloc` (insert the blocks of every pixel's truncation band),
//! `block_assign` (pool blocks for new keys), `depth_tile_max` (the deepest depth of each
//! tile of the image), `block_visible` (the allocated blocks in the frustum that are not wholly
//! hidden behind the surface the tiles they cover measure), `block_list_args` (their count as a
//! dispatch size) and `block_integrate` (one workgroup per visible block). Capacity is explicit: the pool's size comes from a memory
//! budget, and a full pool or hash table is counted on the GPU ([`MapStats`]), never written
//! past: a key without a block reads as unobserved.

use crate::cpu::shared::{
    BLOCK_VOXELS, BRICK_SHIFT, EMPTY_KEY, brick_dims, brick_index, voxel_index, voxel_weight, MAP_COUNTER_BLOCKS_USED, MAP_COUNTER_FREE, MAP_COUNTER_HASH_FULL,
    MAP_COUNTER_OUT_OF_RANGE, MAP_COUNTER_POOL_FULL, MAP_COUNTER_SWAP_IN_REFUSED,
    MAP_COUNTER_SWAPPED_HITS, MAP_COUNTER_VISIBLE, MAP_COUNTERS, block_of_key,
};

pub mod file;
pub mod occupancy;
pub mod swap;
pub mod window;
use crate::tsdf::{TsdfConfig, TsdfStore, VolumeDesc};
use crate::{Error, Gpu, Result};

pub use crate::tsdf::DenseTsdfVolume;

/// Edge of the depth tiles `block_visible` bounds occlusion with, pixels (40 x 30 tiles at
/// 640 x 480): a block's footprint reads a few of them, and a tile's deepest depth is a bound
/// tight enough that blocks hidden behind a surface drop out.
pub const DEPTH_TILE_PX: u32 = 16;

/// `depth_tile_max`'s parameters for a depth image of `k`'s size: tiles of [`DEPTH_TILE_PX`],
/// the grid `block_visible` reads too.
pub fn depth_tile_params(k: &crate::PinholeIntrinsics) -> crate::kernels::depth_tile_max::DepthTileMaxParams {
    crate::kernels::depth_tile_max::DepthTileMaxParams {
        width_px: k.width_px,
        height_px: k.height_px,
        tile_px: DEPTH_TILE_PX,
        tiles_x: k.width_px.div_ceil(DEPTH_TILE_PX),
        tiles_y: k.height_px.div_ceil(DEPTH_TILE_PX),
        ..Default::default()
    }
}

/// Voxels along x, y and z of a sparse map's box: 2048, 2048 and 1023 blocks of 8 (block keys
/// pack 11, 11 and 10 bits; the all-ones key marks a free hash slot).
pub const SPARSE_DIMS_VOXELS: [u32; 3] = [2048 * 8, 2048 * 8, 1023 * 8];
/// Default pool size, blocks of 8³ voxels: 32768 blocks take 64 MiB of TSDF words (and as much
/// colour), what the default dense box takes, and fit WebGPU's default 128 MiB binding.
pub const DEFAULT_POOL_BLOCKS: u32 = 32768;
/// The largest pool every device webfusion opens holds: its voxel words fill WebGPU's default
/// 128 MiB storage binding (the pool's words are one binding, its colour words another). A
/// device that offers larger bindings holds more ([`max_pool_blocks`]).
pub const PORTABLE_MAX_POOL_BLOCKS: u32 = 65536;
/// Default pool size of the native commands, blocks of 8³ voxels: the largest portable pool (its
/// voxel words fill the 128 MiB binding every device webfusion opens has; 261 MiB with colour;
/// `--map-budget-mib` buys more where the device's bindings are larger). A
/// native GPU has the memory, and fine voxels need it: at 6 mm, TUM fr1_rpy's office needs
/// about 49,000 resident blocks, which the browser's default pool cannot hold even with
/// swapping (the camera's view alone fills it). It costs no time at the default voxel size
/// (the per-block kernels skip unused blocks at once).
pub const NATIVE_POOL_BLOCKS: u32 = PORTABLE_MAX_POOL_BLOCKS;
/// Bytes one pool block costs with colour: TSDF and colour words, its surface-brick word, its
/// key, its visible-list and free-list slots and eight hash slots ([`hash_slots_for_pool`]).
pub const BLOCK_BYTES_WITH_COLOR: u64 = BLOCK_VOXELS as u64 * 8 + 4 + 4 + 4 + 4 + 8 * 8;

/// Which kind of map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MapKind {
    /// Every voxel of a box.
    Dense,
    /// Voxel blocks allocated where surfaces are (voxel-block hashing): the default, so the
    /// world grows wherever the camera looks.
    #[default]
    Sparse,
}

impl MapKind {
    /// The name the command line and stats use.
    pub fn name(self) -> &'static str {
        match self {
            Self::Dense => "dense",
            Self::Sparse => "sparse",
        }
    }
}

impl std::str::FromStr for MapKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "dense" => Ok(Self::Dense),
            "sparse" => Ok(Self::Sparse),
            other => Err(Error::InvalidConfig(format!(
                "unknown map kind `{other}`: expected dense or sparse"
            ))),
        }
    }
}

/// The largest pool a device whose storage bindings hold `max_binding_bytes` can hold: its
/// voxel words in one binding (and its colour words in another), at most what
/// [`crate::gpu::LARGEST_STORAGE_BINDING_BYTES`] holds (524,288 blocks).
pub fn max_pool_blocks(max_binding_bytes: u64) -> u32 {
    (max_binding_bytes.min(crate::gpu::LARGEST_STORAGE_BINDING_BYTES) / (4 * u64::from(BLOCK_VOXELS))) as u32
}

/// Pool blocks a memory budget holds (with colour), clamped to [1, `largest`].
pub fn pool_blocks_for_budget(budget_bytes: u64, largest: u32) -> u32 {
    (budget_bytes / BLOCK_BYTES_WITH_COLOR).clamp(1, u64::from(largest.max(1))) as u32
}

/// The pool a memory budget of `budget_mib` MiB buys (the browser's "map memory" setting): an
/// error naming it when it is not a finite number of MiB that holds at least one block;
/// budgets beyond the largest portable pool get that pool, as [`pool_blocks_for_budget`] does
/// (the form is read before a device is chosen, so it offers what every device holds).
pub fn pool_blocks_for_budget_mib(budget_mib: f64) -> Result<u32> {
    let bytes = budget_mib * 1048576.0;
    if !(bytes.is_finite() && bytes >= BLOCK_BYTES_WITH_COLOR as f64) {
        return Err(Error::InvalidConfig(format!("map memory {budget_mib} MiB does not hold a block ({BLOCK_BYTES_WITH_COLOR} bytes)")));
    }
    Ok(pool_blocks_for_budget(bytes as u64, PORTABLE_MAX_POOL_BLOCKS))
}

/// The memory, MiB, of a pool of `pool_blocks` blocks with colour (what
/// [`pool_blocks_for_budget_mib`] turns back into that pool).
pub fn pool_budget_mib(pool_blocks: u32) -> f64 {
    (u64::from(pool_blocks) * BLOCK_BYTES_WITH_COLOR) as f64 / 1048576.0
}

/// Hash slots for a pool: the next power of two at or above eight times its blocks. The table
/// holds the keys of swapped-out blocks too ([`swap`]), so it has room for four pools' worth of
/// blocks while staying at most half full (linear probing's expected probes stay below 2.5).
pub fn hash_slots_for_pool(pool_blocks: u32) -> u32 {
    (8 * pool_blocks).next_power_of_two()
}

/// What a sparse map's counters say (and, with swapping, its host side).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MapStats {
    /// Pool blocks in use (resident on the GPU).
    pub blocks_used: u32,
    /// Pool blocks in all.
    pub pool_blocks: u32,
    /// Blocks the last frame integrated.
    pub visible_blocks: u32,
    /// Block insertions that found no hash slot (cumulative).
    pub hash_full: u32,
    /// Blocks refused for want of pool (cumulative, once per key and frame).
    pub pool_full: u32,
    /// Surface samples outside the map's box (cumulative).
    pub out_of_range: u32,
    /// Blocks swapped in that found no pool block (cumulative; they stay on the host).
    pub swap_in_refused: u32,
    /// Band samples that met a swapped-out block, so were not fused (cumulative).
    pub swapped_hits: u32,
    /// Blocks held in host memory (swapped out), filled in by the swapper.
    pub blocks_on_host: u32,
    /// Bytes those blocks take in host memory.
    pub host_bytes: u64,
    /// Blocks swapped out to the host so far (each time counted).
    pub swapped_out_total: u64,
    /// Blocks swapped back in so far (each time counted).
    pub swapped_in_total: u64,
    /// Times the swapper shrank its regions' margins because the kept region did not fit the
    /// pool ([`swap::MapSwapper::prepare`]).
    pub swap_margin_shrinks: u32,
    /// The regions' margins in force, percent of the full ones (100 without pressure; 0 without
    /// swapping).
    pub swap_margin_percent: u32,
}

impl MapStats {
    /// From the counters' words.
    pub fn from_words(words: &[u32], pool_blocks: u32) -> Self {
        Self {
            blocks_used: words[MAP_COUNTER_BLOCKS_USED] - words[MAP_COUNTER_FREE].min(words[MAP_COUNTER_BLOCKS_USED]),
            pool_blocks,
            visible_blocks: words[MAP_COUNTER_VISIBLE],
            hash_full: words[MAP_COUNTER_HASH_FULL],
            pool_full: words[MAP_COUNTER_POOL_FULL],
            out_of_range: words[MAP_COUNTER_OUT_OF_RANGE],
            swap_in_refused: words[MAP_COUNTER_SWAP_IN_REFUSED],
            swapped_hits: words[MAP_COUNTER_SWAPPED_HITS],
            blocks_on_host: 0,
            host_bytes: 0,
            swapped_out_total: 0,
            swapped_in_total: 0,
            swap_margin_shrinks: 0,
            swap_margin_percent: 0,
        }
    }

    /// Whether some surface could not be stored (the map is incomplete there).
    pub fn exhausted(&self) -> bool {
        self.hash_full > 0 || self.pool_full > 0
    }
}

/// One block of a map, downloaded: its block coordinates in the map's box and its 512 voxel
/// words (and colour words, when colour is fused), x fastest.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MapBlock {
    /// Block coordinates (voxel coordinates / 8).
    pub coords: [u32; 3],
    /// TSDF + weight words.
    pub voxels: Vec<u32>,
    /// RGB8 words (empty without colour).
    pub colors: Vec<u32>,
}

/// What a map's surface costs at two block sizes: its blocks of 8³ as allocated, and the
/// blocks of 16³ (the parents of those) a map of 16³ blocks would have allocated for the same
/// band, with the voxels any frame observed (weight > 0). Allocation along the ±μ band marks a
/// 16³ block wherever it marks one of its 8³ children, so the 16³ count is exact for the same
/// samples; what it leaves out is speed (a 16³ block lets the raycast skip further, and costs
/// a workgroup four times larger or a loop per invocation to integrate).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlockSizeComparison {
    /// Blocks of 8³.
    pub blocks_8: usize,
    /// Blocks of 16³ covering the same blocks of 8³.
    pub blocks_16: usize,
    /// Voxels with a weight.
    pub observed_voxels: u64,
}

impl BlockSizeComparison {
    /// From a map's downloaded blocks.
    pub fn of(blocks: &[MapBlock]) -> Self {
        let parents: std::collections::HashSet<[u32; 3]> = blocks.iter().map(|b| b.coords.map(|c| c >> 1)).collect();
        let observed_voxels = blocks.iter().map(|b| b.voxels.iter().filter(|&&w| voxel_weight(w) > 0).count() as u64).sum();
        Self { blocks_8: blocks.len(), blocks_16: parents.len(), observed_voxels }
    }

    /// Voxels allocated with blocks of 16³ over those with blocks of 8³ (1 to 8).
    pub fn voxel_ratio(&self) -> f64 {
        (8 * self.blocks_16) as f64 / self.blocks_8.max(1) as f64
    }

    /// Fraction of the allocated voxels that were observed, with blocks of 8³ and of 16³.
    pub fn observed_fractions(&self) -> (f64, f64) {
        let allocated = |blocks: usize, voxels: u64| (blocks as u64 * voxels).max(1) as f64;
        (self.observed_voxels as f64 / allocated(self.blocks_8, u64::from(BLOCK_VOXELS)), self.observed_voxels as f64 / allocated(self.blocks_16, 8 * u64::from(BLOCK_VOXELS)))
    }
}

/// A sparse voxel-block map on the GPU.
#[derive(Debug)]
pub struct SparseMap {
    config: TsdfConfig,
    origin_in_world: [f32; 3],
    desc: VolumeDesc,
    voxels: wgpu::Buffer,
    colors: wgpu::Buffer,
    surface_bricks: wgpu::Buffer,
    block_table: wgpu::Buffer,
    block_coords: wgpu::Buffer,
    counters: wgpu::Buffer,
    visible_blocks: wgpu::Buffer,
    free_blocks: wgpu::Buffer,
}

impl SparseMap {
    /// An empty map of `config.pool_blocks` blocks whose box has its voxel (0, 0, 0) corner at
    /// `origin_in_world` (see [`TsdfConfig::origin_for_first_camera`]).
    pub fn new(gpu: &Gpu, config: TsdfConfig, origin_in_world: [f32; 3]) -> Result<Self> {
        config.validate(gpu.limits.max_storage_buffer_binding_size)?;
        let desc = config.desc(origin_in_world);
        let pool = desc.pool_blocks as usize;
        let voxels = gpu.storage_buffer::<u32>("core.map.voxels", pool * BLOCK_VOXELS as usize);
        let colors = gpu.storage_buffer::<u32>(
            "core.map.colors",
            if config.color {
                pool * BLOCK_VOXELS as usize
            } else {
                1
            },
        );
        let surface_bricks = gpu.storage_buffer::<u32>("core.map.surface_bricks", pool);
        let block_table =
            gpu.storage_buffer::<u32>("core.map.block_table", 2 * desc.hash_slots as usize);
        let block_coords = gpu.storage_buffer::<u32>("core.map.block_coords", pool);
        let visible_blocks = gpu.storage_buffer::<u32>("core.map.visible_blocks", pool);
        let free_blocks = gpu.storage_buffer::<u32>("core.map.free_blocks", pool);
        let counters = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("core.map.counters"),
            size: (MAP_COUNTERS * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::INDIRECT
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let map = Self {
            config,
            origin_in_world,
            desc,
            voxels,
            colors,
            surface_bricks,
            block_table,
            block_coords,
            counters,
            visible_blocks,
            free_blocks,
        };
        map.reset(gpu);
        Ok(map)
    }

    /// The settings it was created with.
    pub fn config(&self) -> &TsdfConfig {
        &self.config
    }

    /// The counters (`MAP_COUNTER_*` words; the indirect dispatch size of `block_integrate`).
    pub fn counters(&self) -> &wgpu::Buffer {
        &self.counters
    }

    /// The pool indices of the last frame's visible blocks.
    pub fn visible_blocks(&self) -> &wgpu::Buffer {
        &self.visible_blocks
    }

    /// The free list: pool blocks swapped out and cleared (`MAP_COUNTER_FREE` of them).
    pub fn free_blocks(&self) -> &wgpu::Buffer {
        &self.free_blocks
    }

    /// Reads the counters (waits for the GPU).
    pub async fn stats(&self, gpu: &Gpu) -> Result<MapStats> {
        let words: Vec<u32> = gpu.read_buffer(&self.counters, MAP_COUNTERS).await?;
        Ok(MapStats::from_words(&words, self.desc.pool_blocks))
    }

    /// Downloads every block resident on the GPU, sorted by block key (a canonical order,
    /// whatever order the GPU allocated them in). Waits for the GPU. Blocks swapped out to the
    /// host are not included ([`crate::fusion::mapper::Mapper::download_blocks`] adds them).
    pub async fn download_blocks(&self, gpu: &Gpu) -> Result<Vec<MapBlock>> {
        let words: Vec<u32> = gpu.read_buffer(&self.counters, MAP_COUNTERS).await?;
        let used = words[MAP_COUNTER_BLOCKS_USED] as usize;
        let n = used * BLOCK_VOXELS as usize;
        let keys: Vec<u32> = gpu.read_buffer(&self.block_coords, used).await?;
        let voxels: Vec<u32> = gpu.read_buffer(&self.voxels, n).await?;
        let colors: Vec<u32> = if self.config.color {
            gpu.read_buffer(&self.colors, n).await?
        } else {
            Vec::new()
        };
        let mut order: Vec<usize> = (0..used).filter(|&i| keys[i] != EMPTY_KEY).collect();
        order.sort_by_key(|&i| keys[i]);
        let words = |all: &[u32], i: usize| {
            if all.is_empty() {
                Vec::new()
            } else {
                all[i * BLOCK_VOXELS as usize..(i + 1) * BLOCK_VOXELS as usize].to_vec()
            }
        };
        Ok(order
            .into_iter()
            .map(|i| MapBlock {
                coords: block_of_key(keys[i]),
                voxels: words(&voxels, i),
                colors: words(&colors, i),
            })
            .collect())
    }
}

/// A sparse map's buffers as the host builds them from a list of blocks: block `i` in pool
/// block `i`, its key in the hash table by the kernels' probing.
#[derive(Clone, Debug)]
pub struct PoolImage {
    /// The map's description (its pool and hash table sized for the blocks given).
    pub desc: VolumeDesc,
    /// (key, pool index) per hash slot.
    pub table: Vec<u32>,
    /// Key per pool block.
    pub keys: Vec<u32>,
    /// Voxel words per pool block.
    pub voxels: Vec<u32>,
    /// Colour words per pool block (empty without colour).
    pub colors: Vec<u32>,
    /// Surface-brick word per pool block.
    pub surface: Vec<u32>,
}

impl PoolImage {
    /// Lays `blocks` (any order) out in a pool described by `desc`. More blocks than the pool,
    /// a block outside the box, a block given twice, wrong word counts or a full probe sequence
    /// is an error naming it.
    pub fn from_blocks(desc: VolumeDesc, color: bool, blocks: &[MapBlock]) -> Result<Self> {
        Self::with_swapped(desc, color, blocks, &[])
    }

    /// [`Self::from_blocks`], with the keys of blocks held on the host (`swapped`, block
    /// coordinates) in the table as swapped out, so allocation leaves them alone and swapping
    /// brings them back.
    pub fn with_swapped(desc: VolumeDesc, color: bool, blocks: &[MapBlock], swapped: &[[u32; 3]]) -> Result<Self> {
        Self::lay_out(desc, color, blocks, swapped, true)
    }

    /// The table, keys and surface words of [`Self::from_blocks`], with the voxel and colour
    /// words left empty (what [`SparseMap::replace_blocks`] writes whole).
    fn index_only(desc: VolumeDesc, color: bool, blocks: &[MapBlock]) -> Result<Self> {
        Self::lay_out(desc, color, blocks, &[], false)
    }

    fn lay_out(desc: VolumeDesc, color: bool, blocks: &[MapBlock], swapped: &[[u32; 3]], with_voxels: bool) -> Result<Self> {
        let d = desc;
        let bad = |why: String| Error::InvalidConfig(format!("uploading {} map blocks: {why}", blocks.len()));
        if blocks.len() > d.pool_blocks as usize {
            return Err(bad(format!("the pool holds {} blocks", d.pool_blocks)));
        }
        let n_box = [d.dim_x, d.dim_y, d.dim_z].map(|v| v >> BRICK_SHIFT);
        let mut table = vec![EMPTY_KEY; 2 * d.hash_slots as usize];
        // Puts block `coords`' key into the table with pool index `block`, by the kernels'
        // probing (a resident block's index, or SWAPPED_BLOCK for one held on the host).
        let mut insert = |coords: [u32; 3], block: u32| -> Result<u32> {
            if (0..3).any(|a| coords[a] >= n_box[a]) {
                return Err(bad(format!("block {coords:?} lies outside the box of {n_box:?} blocks")));
            }
            let key = crate::cpu::shared::block_key(coords);
            let Some(s) = crate::cpu::shared::probe_slot(&table, &d, coords) else {
                return Err(bad(format!("no hash slot within {} probes of block {coords:?}", crate::cpu::shared::MAP_MAX_PROBES)));
            };
            if table[2 * s] == key {
                return Err(bad(format!("block {coords:?} is given twice")));
            }
            table[2 * s] = key;
            table[2 * s + 1] = block;
            Ok(key)
        };
        let mut keys = vec![EMPTY_KEY; d.pool_blocks as usize];
        let voxel_words = BLOCK_VOXELS as usize;
        let copied = if with_voxels { blocks.len() } else { 0 };
        let mut voxels = vec![0u32; copied * voxel_words];
        let mut colors = vec![0u32; if color { copied * voxel_words } else { 0 }];
        let mut surface = vec![0u32; blocks.len()];
        for (i, block) in blocks.iter().enumerate() {
            if block.voxels.len() != voxel_words || (color && block.colors.len() != voxel_words) {
                return Err(bad(format!("block {:?} has {} voxel and {} colour words, not {voxel_words}", block.coords, block.voxels.len(), block.colors.len())));
            }
            keys[i] = insert(block.coords, i as u32)?;
            if with_voxels {
                voxels[i * voxel_words..(i + 1) * voxel_words].copy_from_slice(&block.voxels);
                if color {
                    colors[i * voxel_words..(i + 1) * voxel_words].copy_from_slice(&block.colors);
                }
            }
            surface[i] = surface_word(&block.voxels);
        }
        for &coords in swapped {
            insert(coords, crate::cpu::shared::SWAPPED_BLOCK)?;
        }
        Ok(Self { desc, table, keys, voxels, colors, surface })
    }
}

impl SparseMap {
    /// Replaces the map's contents with `blocks` (as [`Self::download_blocks`] gives them; any
    /// order): block `i` goes to pool block `i`, its key into the hash table by the probing the
    /// kernels use. More blocks than the pool, a block outside the box or a full probe sequence
    /// is an error and leaves the map empty.
    pub fn upload_blocks(&self, gpu: &Gpu, blocks: &[MapBlock]) -> Result<()> {
        self.upload_blocks_swapped(gpu, blocks, &[])
    }

    /// [`Self::upload_blocks`], with the keys of blocks the host holds (`swapped`) marked as
    /// swapped out in the table.
    pub fn upload_blocks_swapped(&self, gpu: &Gpu, blocks: &[MapBlock], swapped: &[[u32; 3]]) -> Result<()> {
        self.reset(gpu);
        let image = PoolImage::with_swapped(self.desc, self.config.color, blocks, swapped)?;
        gpu.write_buffer(&self.voxels, &image.voxels);
        if self.config.color {
            gpu.write_buffer(&self.colors, &image.colors);
        }
        self.write_index(gpu, &image, blocks.len());
        Ok(())
    }

    /// Writes an image's hash table, keys and surface words, and `blocks_used` as the pool's
    /// used count (its other counters zero).
    fn write_index(&self, gpu: &Gpu, image: &PoolImage, blocks_used: usize) {
        gpu.write_buffer(&self.block_table, &image.table);
        gpu.write_buffer(&self.block_coords, &image.keys);
        gpu.write_buffer(&self.surface_bricks, &image.surface);
        let mut counters = [0u32; MAP_COUNTERS];
        counters[MAP_COUNTER_BLOCKS_USED] = blocks_used as u32;
        gpu.write_buffer(&self.counters, &counters);
    }

    /// Makes the pool hold `blocks` (block `i` in pool block `i`) when it held them already
    /// except at the pool blocks `replaced`: writes the hash table, keys and surface words
    /// whole, and the voxels (and colours) of the replaced blocks only. A window moving over a
    /// larger map ([`window::MapWindow`]) keeps most of its blocks; this writes what changed.
    /// The same errors as [`Self::upload_blocks`]; after one the pool's contents are undefined
    /// (upload it whole again).
    pub fn replace_blocks(&self, gpu: &Gpu, blocks: &[MapBlock], replaced: &[usize]) -> Result<()> {
        // Checks every block's word counts too.
        let image = PoolImage::index_only(self.desc, self.config.color, blocks)?;
        if let Some(&i) = replaced.iter().find(|&&i| i >= blocks.len()) {
            return Err(Error::InvalidConfig(format!("replacing pool block {i} of {}", blocks.len())));
        }
        self.write_index(gpu, &image, blocks.len());
        let block_bytes = u64::from(BLOCK_VOXELS) * 4;
        for &i in replaced {
            gpu.queue.write_buffer(&self.voxels, i as u64 * block_bytes, bytemuck::cast_slice(&blocks[i].voxels));
            if self.config.color {
                gpu.queue.write_buffer(&self.colors, i as u64 * block_bytes, bytemuck::cast_slice(&blocks[i].colors));
            }
        }
        Ok(())
    }

    /// Where the box's voxel (0, 0, 0) corner lies in the world (what [`Self::new`] was given).
    pub fn origin_in_world(&self) -> [f32; 3] {
        self.origin_in_world
    }
}

/// The surface-brick word of a block's voxels: 1 when a voxel holds an observed TSDF below
/// FAR_TSDF (a surface or its band may lie in it).
pub fn surface_word(voxels: &[u32]) -> u32 {
    let far = crate::cpu::shared::FAR_TSDF;
    u32::from(voxels.iter().any(|&w| voxel_weight(w) > 0 && crate::cpu::shared::voxel_tsdf(w) < far))
}

/// Voxel coordinates of voxel `v` (x fastest) of the 8³ block at block coordinates `block`: the
/// inverse of `voxel_in_block`.
fn block_voxel(block: [u32; 3], v: u32) -> [u32; 3] {
    [(block[0] << BRICK_SHIFT) + (v & 7), (block[1] << BRICK_SHIFT) + ((v >> 3) & 7), (block[2] << BRICK_SHIFT) + (v >> 6)]
}

/// Index of voxel `[x, y, z]` in a dense box's words, or `None` past the box's edge.
fn dense_index(d: &VolumeDesc, [x, y, z]: [u32; 3]) -> Option<usize> {
    (x < d.dim_x && y < d.dim_y && z < d.dim_z).then(|| voxel_index(d, x, y, z) as usize)
}

/// A dense box's observed 8³ tiles (its surface bricks) as blocks, in key order (voxels past the
/// box's edge read 0). Waits for the GPU.
pub async fn dense_blocks(gpu: &Gpu, dense: &DenseTsdfVolume) -> Result<Vec<MapBlock>> {
    let d = dense.desc();
    let n = d.voxel_count();
    let voxels: Vec<u32> = gpu.read_buffer(dense.voxels(), n).await?;
    let colors: Vec<u32> = if dense.has_color() { gpu.read_buffer(dense.colors(), n).await? } else { Vec::new() };
    let tiles = brick_dims(&d);
    let mut blocks = Vec::new();
    for bz in 0..tiles[2] {
        for by in 0..tiles[1] {
            for bx in 0..tiles[0] {
                let mut block = MapBlock { coords: [bx, by, bz], voxels: vec![0; BLOCK_VOXELS as usize], colors: if colors.is_empty() { Vec::new() } else { vec![0; BLOCK_VOXELS as usize] } };
                for v in 0..BLOCK_VOXELS {
                    if let Some(i) = dense_index(&d, block_voxel(block.coords, v)) {
                        block.voxels[v as usize] = voxels[i];
                        if !colors.is_empty() {
                            block.colors[v as usize] = colors[i];
                        }
                    }
                }
                if block.voxels.iter().any(|&w| voxel_weight(w) > 0) {
                    blocks.push(block);
                }
            }
        }
    }
    Ok(blocks)
}

/// Replaces a dense box's contents with `blocks` (8³ tiles; voxels past the box's edge are
/// ignored, tiles not given are unobserved). A tile outside the box or with the wrong word
/// counts is an error and leaves the box empty.
pub fn upload_dense_blocks(gpu: &Gpu, dense: &DenseTsdfVolume, blocks: &[MapBlock]) -> Result<()> {
    dense.reset(gpu);
    let d = dense.desc();
    let tiles = brick_dims(&d);
    let n = d.voxel_count();
    let mut voxels = vec![0u32; n];
    let mut colors = vec![0u32; if dense.has_color() { n } else { 0 }];
    let mut bricks = vec![0u32; d.brick_count()];
    for b in blocks {
        if (0..3).any(|a| b.coords[a] >= tiles[a]) || b.voxels.len() != BLOCK_VOXELS as usize || (dense.has_color() && b.colors.len() != BLOCK_VOXELS as usize) {
            dense.reset(gpu);
            return Err(Error::InvalidConfig(format!("uploading {} blocks into a {:?} box: block {:?} lies outside it or has the wrong word counts", blocks.len(), [d.dim_x, d.dim_y, d.dim_z], b.coords)));
        }
        for v in 0..BLOCK_VOXELS {
            if let Some(i) = dense_index(&d, block_voxel(b.coords, v)) {
                voxels[i] = b.voxels[v as usize];
                if dense.has_color() {
                    colors[i] = b.colors[v as usize];
                }
            }
        }
        let [x, y, z] = block_voxel(b.coords, 0);
        bricks[brick_index(&d, x, y, z) as usize] = surface_word(&b.voxels);
    }
    gpu.write_buffer(dense.voxels(), &voxels);
    if dense.has_color() {
        gpu.write_buffer(dense.colors(), &colors);
    }
    gpu.write_buffer(dense.surface_bricks(), &bricks);
    Ok(())
}

/// The mesh of a sparse map given as blocks (a swapping map's, gathered from the GPU and the
/// host): on the GPU in a temporary map holding just these blocks when it fits one binding,
/// else by the CPU references of the same kernels.
pub async fn mesh_of_blocks(gpu: &Gpu, config: &TsdfConfig, origin_in_world: [f32; 3], blocks: &[MapBlock]) -> Result<crate::mesh::Mesh> {
    let n = u32::try_from(blocks.len()).unwrap_or(u32::MAX).max(1);
    let config = TsdfConfig { pool_blocks: n, swap: false, kind: MapKind::Sparse, ..*config };
    if config.validate(gpu.limits.max_storage_buffer_binding_size).is_ok() {
        let map = SparseMap::new(gpu, config, origin_in_world)?;
        map.upload_blocks(gpu, blocks)?;
        return crate::mesh::extract_mesh(gpu, &map).await;
    }
    let image = PoolImage::from_blocks(config.desc(origin_in_world), config.color, blocks)?;
    let soup = crate::mesh::extract_map_triangles_cpu(&image.voxels, config.color.then_some(image.colors.as_slice()), &image.table, &image.keys, &image.desc)?;
    Ok(crate::mesh::Mesh::from_triangle_soup(&soup))
}

/// The configuration a saved map (`header`) is loaded with: its kind, voxels, band, weights and
/// colour; a dense map's box, or a sparse map's pool of `pool_blocks` blocks (no swapping).
pub fn saved_map_config(header: &file::MapFileHeader, pool_blocks: u32) -> TsdfConfig {
    TsdfConfig {
        kind: header.kind,
        dims_voxels: header.dims_voxels,
        voxel_size_m: header.voxel_size_m,
        truncation_m: header.truncation_m,
        noise_band_sigmas: header.noise_band_sigmas,
        max_weight: header.max_weight,
        color: header.color,
        swap: false,
        pool_blocks,
        ..TsdfConfig::default()
    }
}

/// A map holding every one of `blocks` on the GPU, with the settings and placement of a saved
/// map's `header`: a sparse map's pool just large enough for them (one binding), a dense box as
/// it was saved. What a virtual sensor renders from. A sparse map larger than one binding is
/// [`Error::InvalidConfig`] naming the sizes.
pub fn resident_map(gpu: &Gpu, header: &file::MapFileHeader, blocks: &[MapBlock]) -> Result<Map> {
    match header.kind {
        MapKind::Dense => {
            let config = saved_map_config(header, 1);
            let map = Map::new(gpu, config, header.origin_in_world)?;
            let Map::Dense(dense) = &map else { unreachable!("a dense config makes a dense map") };
            upload_dense_blocks(gpu, dense, blocks)?;
            Ok(map)
        }
        MapKind::Sparse => {
            let n = u32::try_from(blocks.len()).unwrap_or(u32::MAX).max(1);
            let config = saved_map_config(header, n);
            if config.validate(gpu.limits.max_storage_buffer_binding_size).is_err() {
                return Err(Error::InvalidConfig(format!(
                    "the map's {} blocks do not fit one GPU binding of this device ({} blocks of {} KiB at most, {} MiB): rendering it needs it all on the GPU (fuse it with larger voxels, a shorter --max-depth, or --noise-band-sigmas 0, whose narrower band at far range takes fewer blocks)",
                    blocks.len(),
                    max_pool_blocks(gpu.limits.max_storage_buffer_binding_size),
                    4 * crate::cpu::shared::BLOCK_VOXELS / 1024,
                    gpu.limits.max_storage_buffer_binding_size >> 20
                )));
            }
            let map = SparseMap::new(gpu, config, header.origin_in_world)?;
            map.upload_blocks(gpu, blocks)?;
            Ok(Map::Sparse(map))
        }
    }
}

impl TsdfStore for SparseMap {
    fn desc(&self) -> VolumeDesc {
        self.desc
    }
    fn voxels(&self) -> &wgpu::Buffer {
        &self.voxels
    }
    fn colors(&self) -> &wgpu::Buffer {
        &self.colors
    }
    fn surface_bricks(&self) -> &wgpu::Buffer {
        &self.surface_bricks
    }
    fn block_table(&self) -> &wgpu::Buffer {
        &self.block_table
    }
    fn block_coords(&self) -> &wgpu::Buffer {
        &self.block_coords
    }
    fn has_color(&self) -> bool {
        self.config.color
    }
    fn reset(&self, gpu: &Gpu) {
        // Free slots and unused pool blocks hold EMPTY_KEY (a key past the box: marching cubes
        // finds no cell in such a block).
        gpu.fill_buffer(&self.block_table, EMPTY_KEY);
        gpu.fill_buffer(&self.block_coords, EMPTY_KEY);
        let mut encoder = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("core.map.reset"),
            });
        for b in [
            &self.voxels,
            &self.colors,
            &self.surface_bricks,
            &self.counters,
            &self.visible_blocks,
            &self.free_blocks,
        ] {
            encoder.clear_buffer(b, 0, None);
        }
        gpu.queue.submit([encoder.finish()]);
    }
    fn memory_bytes(&self) -> u64 {
        [
            &self.voxels,
            &self.colors,
            &self.surface_bricks,
            &self.block_table,
            &self.block_coords,
            &self.counters,
            &self.visible_blocks,
            &self.free_blocks,
        ]
        .iter()
        .map(|b| b.size())
        .sum()
    }
}

/// A map of either kind.
#[derive(Debug)]
pub enum Map {
    /// Every voxel of a box.
    Dense(DenseTsdfVolume),
    /// Voxel blocks where surfaces are.
    Sparse(SparseMap),
}

impl Map {
    /// An empty map of `config.kind`, its box's voxel (0, 0, 0) corner at `origin_in_world`.
    pub fn new(gpu: &Gpu, config: TsdfConfig, origin_in_world: [f32; 3]) -> Result<Self> {
        Ok(match config.kind {
            MapKind::Dense => Self::Dense(DenseTsdfVolume::new(gpu, config, origin_in_world)?),
            MapKind::Sparse => Self::Sparse(SparseMap::new(gpu, config, origin_in_world)?),
        })
    }

    /// The sparse map, if it is one.
    pub fn sparse(&self) -> Option<&SparseMap> {
        match self {
            Self::Sparse(m) => Some(m),
            Self::Dense(_) => None,
        }
    }

    fn store(&self) -> &dyn TsdfStore {
        match self {
            Self::Dense(m) => m,
            Self::Sparse(m) => m,
        }
    }
}

impl TsdfStore for Map {
    fn desc(&self) -> VolumeDesc {
        self.store().desc()
    }
    fn voxels(&self) -> &wgpu::Buffer {
        self.store().voxels()
    }
    fn colors(&self) -> &wgpu::Buffer {
        self.store().colors()
    }
    fn surface_bricks(&self) -> &wgpu::Buffer {
        self.store().surface_bricks()
    }
    fn block_table(&self) -> &wgpu::Buffer {
        self.store().block_table()
    }
    fn block_coords(&self) -> &wgpu::Buffer {
        self.store().block_coords()
    }
    fn has_color(&self) -> bool {
        self.store().has_color()
    }
    fn reset(&self, gpu: &Gpu) {
        self.store().reset(gpu);
    }
    fn memory_bytes(&self) -> u64 {
        self.store().memory_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_sizes_compare_by_the_parents_the_blocks_share() {
        let block = |coords: [u32; 3], observed: usize| MapBlock { coords, voxels: (0..BLOCK_VOXELS as usize).map(|i| if i < observed { 1 << 16 } else { 0 }).collect(), colors: Vec::new() };
        // A wall one block thick along x at z = 0: pairs of 8³ blocks share a 16³ parent in x
        // and y; the odd block out at x = 4 has one of its own.
        let mut blocks: Vec<MapBlock> = (0..5).flat_map(|x| (0..2).map(move |y| block([x, y, 0], 64))).collect();
        blocks.push(block([9, 9, 9], 512));
        let c = BlockSizeComparison::of(&blocks);
        assert_eq!((c.blocks_8, c.blocks_16, c.observed_voxels), (11, 4, 10 * 64 + 512));
        assert!((c.voxel_ratio() - 32.0 / 11.0).abs() < 1e-12);
        let (f8, f16) = c.observed_fractions();
        assert!((f8 - 1152.0 / (11.0 * 512.0)).abs() < 1e-12 && (f16 - 1152.0 / (4.0 * 4096.0)).abs() < 1e-12, "{f8} {f16}");
        let none = BlockSizeComparison::of(&[]);
        assert_eq!((none.blocks_16, none.observed_fractions()), (0, (0.0, 0.0)), "an empty map divides by nothing");
    }

    #[test]
    fn a_memory_budget_in_mib_buys_its_pool_and_bad_ones_are_named() {
        // The browser's default and largest pools, through the MiB the form shows (one decimal).
        for pool in [DEFAULT_POOL_BLOCKS, PORTABLE_MAX_POOL_BLOCKS] {
            let shown: f64 = format!("{:.1}", pool_budget_mib(pool)).parse().expect("a number");
            assert_eq!(pool_blocks_for_budget_mib(shown).expect("a budget"), pool, "{shown} MiB");
        }
        assert_eq!(pool_blocks_for_budget_mib(100_000.0).expect("a budget"), PORTABLE_MAX_POOL_BLOCKS, "beyond the largest pool: the largest");
        assert_eq!(pool_blocks_for_budget(100_000 << 20, 200_000), 200_000, "a device's largest pool caps a native budget");
        assert_eq!(max_pool_blocks(crate::gpu::REQUIRED_STORAGE_BINDING_BYTES), PORTABLE_MAX_POOL_BLOCKS, "WebGPU's default binding: the portable pool");
        assert_eq!(max_pool_blocks(u64::MAX), 524_288, "at most what the largest binding requested holds");
        assert_eq!(pool_blocks_for_budget_mib(0.01).expect("a budget"), 2, "10 KiB: two blocks");
        for bad in [0.0, -5.0, 0.001, f64::NAN, f64::INFINITY] {
            let err = pool_blocks_for_budget_mib(bad).expect_err("not a budget").to_string();
            assert!(err.contains("map memory") && err.contains("MiB"), "{bad}: {err}");
        }
    }
}
