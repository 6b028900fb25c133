//! Coordinate -> voxel lookups for the level-based measures (surface detail,
//! colour neighbourhoods): a hash map on packed coordinates with a
//! multiplicative hasher, because these measures do tens of millions of
//! lookups per shape and SipHash would dominate them.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use glam::IVec3;

/// Fibonacci hashing of one u64 key (the only thing ever hashed here).
#[derive(Default)]
pub(crate) struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_u64(&mut self, k: u64) {
        let h = k.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 = h ^ (h >> 29);
    }
}

/// Voxel coordinates (21 bits per axis, offset so negatives pack) -> index.
pub(crate) struct VoxelIndex {
    map: HashMap<u64, u32, BuildHasherDefault<KeyHasher>>,
}

const BIAS: i32 = 1 << 20;

fn pack(c: IVec3) -> Option<u64> {
    let ok = |v: i32| (-BIAS..BIAS).contains(&v);
    (ok(c.x) && ok(c.y) && ok(c.z))
        .then(|| ((c.x + BIAS) as u64) | ((c.y + BIAS) as u64) << 21 | ((c.z + BIAS) as u64) << 42)
}

impl VoxelIndex {
    pub(crate) fn new(coords: impl Iterator<Item = IVec3>) -> Self {
        let mut map = HashMap::with_hasher(BuildHasherDefault::<KeyHasher>::default());
        for (i, c) in coords.enumerate() {
            if let Some(k) = pack(c) {
                map.entry(k).or_insert(i as u32);
            }
        }
        VoxelIndex { map }
    }

    pub(crate) fn get(&self, c: IVec3) -> Option<usize> {
        self.map.get(&pack(c)?).map(|&i| i as usize)
    }
}
