//! Batched voxel keys: (batch item, x, y, z) in one `u64`, sorted by item then x, y,
//! z (see the parent module for the packing and why neighbour arithmetic is exact).

use super::*;

#[inline]
pub(super) fn in_range(c: IVec3) -> bool {
    c.cmpge(IVec3::splat(-COORD_LIMIT)).all() && c.cmplt(IVec3::splat(COORD_LIMIT)).all()
}

/// Packs a voxel of batch item `batch` into a key (no range check).
#[inline]
pub fn pack_key(batch: u32, c: IVec3) -> u64 {
    ((batch as u64) << 48)
        | (((c.x + BIAS) as u64) << 32)
        | (((c.y + BIAS) as u64) << 16)
        | ((c.z + BIAS) as u64)
}

/// Inverse of [`pack_key`]: (batch, coordinate).
#[inline]
pub fn unpack_key(k: u64) -> (u32, IVec3) {
    (
        (k >> 48) as u32,
        IVec3::new(
            ((k >> 32) & FIELD_MASK) as i32 - BIAS,
            ((k >> 16) & FIELD_MASK) as i32 - BIAS,
            (k & FIELD_MASK) as i32 - BIAS,
        ),
    )
}

/// The key difference of a coordinate offset, to be added with `wrapping_add`.
#[inline]
pub(super) fn key_delta(d: IVec3) -> u64 {
    ((d.x as i64) * (1i64 << 32) + (d.y as i64) * (1i64 << 16) + d.z as i64) as u64
}

#[inline]
pub(super) fn strip_batch(k: u64) -> u64 {
    k & ((1u64 << 48) - 1)
}
