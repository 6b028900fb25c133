//! The 26-connected components of a voxel set: the pieces of a shape, the
//! specks removed from a level, the regions where two shapes differ.

use glam::IVec3;

use super::VoxelMap;

/// The 26 neighbours of a voxel (every offset in -1..=1 but the voxel).
/// Sizes of the 26-connected components of a voxel set, largest first.
pub fn components(coords: &[IVec3]) -> Vec<usize> {
    let (_, mut sizes) = component_labels(coords);
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    sizes
}

/// The 26-connected components of a voxel set: per voxel, its component's
/// index, and per component its size (in the order first met).
pub fn component_labels(coords: &[IVec3]) -> (Vec<usize>, Vec<usize>) {
    let index: VoxelMap<usize> = coords.iter().enumerate().map(|(i, &c)| (c, i)).collect();
    let mut label = vec![usize::MAX; coords.len()];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..coords.len() {
        if label[start] != usize::MAX {
            continue;
        }
        let id = sizes.len();
        label[start] = id;
        stack.push(start);
        let mut size = 0;
        while let Some(i) = stack.pop() {
            size += 1;
            for d in NEIGHBOURS_26 {
                if let Some(&j) = index.get(coords[i] + d) {
                    if label[j] == usize::MAX {
                        label[j] = id;
                        stack.push(j);
                    }
                }
            }
        }
        sizes.push(size);
    }
    (label, sizes)
}

pub const NEIGHBOURS_26: [IVec3; 26] = {
    let mut out = [IVec3::ZERO; 26];
    let mut k = 0;
    let mut i = 0;
    while i < 27 {
        let d = IVec3::new(i % 3 - 1, (i / 3) % 3 - 1, i / 9 - 1);
        if !(d.x == 0 && d.y == 0 && d.z == 0) {
            out[k] = d;
            k += 1;
        }
        i += 1;
    }
    out
};
