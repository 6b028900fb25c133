//! Morton keys: a voxel's (i, j, k) interleaved, i in the most significant bit, so that
//! a parent's key is its children's `key >> 3` and sorting keys sorts parents first.

use super::*;

/// Spreads the low 21 bits of `x` to every third bit.
pub(super) fn spread_bits(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// Inverse of [`spread_bits`].
pub(super) fn compact_bits(x: u64) -> u64 {
    let mut x = x & 0x1249_2492_4924_9249;
    x = (x ^ (x >> 2)) & 0x10c3_0c30_c30c_30c3;
    x = (x ^ (x >> 4)) & 0x100f_00f0_0f00_f00f;
    x = (x ^ (x >> 8)) & 0x1f_0000_ff00_00ff;
    x = (x ^ (x >> 16)) & 0x1f_0000_0000_ffff;
    x = (x ^ (x >> 32)) & 0x1f_ffff;
    x
}

/// Morton key of voxel (i, j, k): i in the most significant interleaved bit, so the
/// parent's key is `key >> 3` and sorting by key sorts by parent first.
pub(super) fn morton(i: u32, j: u32, k: u32) -> u64 {
    spread_bits(i as u64) << 2 | spread_bits(j as u64) << 1 | spread_bits(k as u64)
}

pub(super) fn morton_decode(key: u64) -> IVec3 {
    IVec3::new(compact_bits(key >> 2) as i32, compact_bits(key >> 1) as i32, compact_bits(key) as i32)
}

/// Centre of the voxel with Morton key `key` at `resolution`, normalised units.
pub(super) fn voxel_centre(key: u64, resolution: u32) -> DVec3 {
    crate::grid::GridTransform { resolution, frame: Default::default() }.centre_normalised(morton_decode(key))
}
