//! Coordinate -> voxel lookups for the level-based measures (surface detail,
//! colour neighbourhoods): the meshers' packed-key hash map (a multiplicative
//! hasher: these measures do tens of millions of lookups per shape, and SipHash
//! would dominate them).

use glam::IVec3;

use crate::recon::spatial::{pack, KeyMap, KEY_LIMIT};

/// Voxel coordinates -> index of the first voxel with them.
pub(crate) struct VoxelIndex {
    map: KeyMap<u32>,
}

/// The packed key of `c`; None outside the range keys keep apart.
fn key(c: IVec3) -> Option<u64> {
    let limit = IVec3::splat(KEY_LIMIT);
    (c.cmpge(-limit).all() && c.cmple(limit).all()).then(|| pack(c.to_array()))
}

impl VoxelIndex {
    pub(crate) fn new(coords: impl Iterator<Item = IVec3>) -> Self {
        let mut map = KeyMap::default();
        for (i, c) in coords.enumerate() {
            if let Some(k) = key(c) {
                map.entry(k).or_insert(i as u32);
            }
        }
        VoxelIndex { map }
    }

    pub(crate) fn get(&self, c: IVec3) -> Option<usize> {
        self.map.get(&key(c)?).map(|&i| i as usize)
    }
}
