//! Voxel keys: integer coordinates packed into one `u64` (21 bits a
//! component, biased), hashed by a small multiplicative hasher. The std
//! SipHash is several times slower for the tens of millions of lookups the
//! meshers and the level measures make, and these keys need no protection
//! against chosen collisions.
//!
//! The tensor side keys voxels of a batch of grids in its own packing
//! ([`crate::learn::grid::pack_key`]: batch item, then 16 bits a component,
//! so that sorting keys sorts by item then x, y, z, as its kernel maps
//! need); the encoder orders voxels by Morton code (parents before
//! children). Everything else uses these keys.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use glam::IVec3;

/// A small multiplicative hasher for packed integer keys.
#[derive(Default, Clone, Copy)]
pub struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 ^= self.0 >> 29;
    }
}

/// A hash map over packed keys ([`pack`]).
pub type KeyMap<V> = HashMap<u64, V, BuildHasherDefault<KeyHasher>>;

const KEY_BITS: u32 = 21;
const KEY_BIAS: i64 = 1 << (KEY_BITS - 1);
const KEY_MASK: u64 = (1 << KEY_BITS) - 1;

/// Largest coordinate magnitude [`pack`] keeps apart: keys of coordinates in
/// [-KEY_LIMIT, KEY_LIMIT] are distinct.
pub const KEY_LIMIT: i32 = (KEY_BIAS - 1) as i32;

/// Packs integer coordinates in [-2^20, 2^20) into one key (no range check:
/// callers keep coordinates within [`KEY_LIMIT`], or use [`VoxelMap`]).
#[inline]
pub fn pack(c: [i32; 3]) -> u64 {
    let f = |v: i32| ((v as i64 + KEY_BIAS) as u64) & KEY_MASK;
    (f(c[0]) << (2 * KEY_BITS)) | (f(c[1]) << KEY_BITS) | f(c[2])
}

/// Inverse of [`pack`].
#[inline]
pub fn unpack(k: u64) -> [i32; 3] {
    let f = |v: u64| ((v & KEY_MASK) as i64 - KEY_BIAS) as i32;
    [f(k >> (2 * KEY_BITS)), f(k >> KEY_BITS), f(k)]
}

#[inline]
fn in_range(c: IVec3) -> bool {
    let limit = IVec3::splat(KEY_LIMIT);
    c.cmpge(-limit).all() && c.cmple(limit).all()
}

/// A map from voxel coordinates to values: packed keys and [`KeyHasher`]
/// for every coordinate [`pack`] keeps apart, a plain map for the rare ones
/// past it (a level edited far out), so it is exact for any coordinate.
#[derive(Clone, Debug)]
pub struct VoxelMap<V> {
    packed: KeyMap<V>,
    far: HashMap<IVec3, V>,
}

impl<V> Default for VoxelMap<V> {
    fn default() -> Self {
        VoxelMap { packed: KeyMap::default(), far: HashMap::new() }
    }
}

impl<V> VoxelMap<V> {
    pub fn with_capacity(n: usize) -> Self {
        VoxelMap { packed: KeyMap::with_capacity_and_hasher(n, Default::default()), far: HashMap::new() }
    }

    /// Inserts, returning the value `c` had.
    pub fn insert(&mut self, c: IVec3, v: V) -> Option<V> {
        if in_range(c) {
            self.packed.insert(pack(c.to_array()), v)
        } else {
            self.far.insert(c, v)
        }
    }

    /// Inserts unless `c` already has a value.
    pub fn insert_if_absent(&mut self, c: IVec3, v: V) {
        if in_range(c) {
            self.packed.entry(pack(c.to_array())).or_insert(v);
        } else {
            self.far.entry(c).or_insert(v);
        }
    }

    #[inline]
    pub fn get(&self, c: IVec3) -> Option<&V> {
        if in_range(c) {
            self.packed.get(&pack(c.to_array()))
        } else {
            self.far.get(&c)
        }
    }

    pub fn contains(&self, c: IVec3) -> bool {
        self.get(c).is_some()
    }

    pub fn len(&self) -> usize {
        self.packed.len() + self.far.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Later pairs replace earlier ones, as for a `HashMap`.
impl<V> FromIterator<(IVec3, V)> for VoxelMap<V> {
    fn from_iter<I: IntoIterator<Item = (IVec3, V)>>(iter: I) -> Self {
        let iter = iter.into_iter();
        let mut map = VoxelMap::with_capacity(iter.size_hint().0);
        for (c, v) in iter {
            map.insert(c, v);
        }
        map
    }
}

/// Voxel coordinates -> index of the first voxel with them (a level's rows,
/// or a subset's positions).
#[derive(Clone, Debug, Default)]
pub struct VoxelIndex {
    map: VoxelMap<u32>,
}

impl VoxelIndex {
    pub fn new(coords: impl Iterator<Item = IVec3>) -> Self {
        let mut map = VoxelMap::with_capacity(coords.size_hint().0);
        for (i, c) in coords.enumerate() {
            map.insert_if_absent(c, i as u32);
        }
        VoxelIndex { map }
    }

    #[inline]
    pub fn get(&self, c: IVec3) -> Option<usize> {
        self.map.get(c).map(|&i| i as usize)
    }

    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip_and_stay_apart_up_to_the_limit() {
        for c in [[0, 0, 0], [-1, 2, -3], [KEY_LIMIT, -KEY_LIMIT, 7], [-KEY_LIMIT - 1, 0, 0]] {
            assert_eq!(unpack(pack(c)), c);
        }
        assert_ne!(pack([KEY_LIMIT, 0, 0]), pack([-KEY_LIMIT, 0, 0]));
    }

    #[test]
    fn a_voxel_map_is_exact_past_the_packed_range() {
        let far = IVec3::new(KEY_LIMIT + 1, 0, 0);
        // `far` packs onto the key of (-2^20, 0, 0): the map must keep them apart.
        assert_eq!(pack(far.to_array()), pack([-KEY_LIMIT - 1, 0, 0]));
        let mut m: VoxelMap<u32> = [(IVec3::new(-KEY_LIMIT - 1, 0, 0), 1), (IVec3::new(3, -4, 5), 2)].into_iter().collect();
        assert_eq!(m.get(far), None);
        m.insert(far, 3);
        assert_eq!((m.get(far), m.get(IVec3::new(-KEY_LIMIT - 1, 0, 0)), m.get(IVec3::new(3, -4, 5))), (Some(&3), Some(&1), Some(&2)));
        assert_eq!(m.insert(far, 4), Some(3), "later values replace earlier ones");
        assert_eq!(m.len(), 3);
        let index = VoxelIndex::new([IVec3::ONE, IVec3::ZERO, IVec3::ONE].into_iter());
        assert_eq!((index.get(IVec3::ONE), index.get(IVec3::ZERO), index.get(IVec3::NEG_ONE)), (Some(0), Some(1), None));
    }
}
