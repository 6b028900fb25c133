use super::*;
use std::collections::{HashMap, HashSet};

use crate::util::rng::Rng;

fn random_coords(rng: &mut Rng, n: usize, lo: i32, size: i32) -> Vec<IVec3> {
    (0..n)
        .map(|_| IVec3::new(lo + rng.below(size as usize) as i32, lo + rng.below(size as usize) as i32, lo + rng.below(size as usize) as i32))
        .collect()
}

#[test]
fn keys_round_trip_and_sort_order() {
    for c in [IVec3::new(-16384, 0, 16383), IVec3::new(5, -7, 9), IVec3::ZERO] {
        for b in [0u32, 3, 65535] {
            assert_eq!(unpack_key(pack_key(b, c)), (b, c));
        }
    }
    assert!(pack_key(0, IVec3::new(0, 9, 9)) < pack_key(0, IVec3::new(1, -9, -9)));
    assert!(pack_key(0, IVec3::new(0, 0, 9)) < pack_key(0, IVec3::new(0, 1, -9)));
    assert!(pack_key(0, IVec3::splat(100)) < pack_key(1, IVec3::splat(-100)));
    let k = pack_key(2, IVec3::new(3, -4, 5));
    assert_eq!(k.wrapping_add(key_delta(IVec3::new(-2, 2, -1))), pack_key(2, IVec3::new(1, -2, 4)));
    assert!(SparseGrid::from_coords(16, &[IVec3::new(COORD_LIMIT, 0, 0)]).is_err());
}

#[test]
fn from_coords_sorts_dedups_and_orders() {
    let coords = [IVec3::new(2, 0, 0), IVec3::new(0, 1, 0), IVec3::new(0, 0, 5), IVec3::new(0, 1, 0)];
    let g = SparseGrid::from_coords(8, &coords).unwrap();
    assert_eq!(g.coords(), vec![IVec3::new(0, 0, 5), IVec3::new(0, 1, 0), IVec3::new(2, 0, 0)]);
    assert!(matches!(SparseGrid::from_unique_coords(8, &coords), Err(GridError::Duplicate(_))));
    let (g, order) = SparseGrid::from_unique_coords(8, &coords[..3]).unwrap();
    assert_eq!(order, vec![2, 1, 0]);
    assert_eq!(g.find(IVec3::new(0, 1, 0), 0), Some(1));
    assert_eq!(g.find(IVec3::new(1, 1, 0), 0), None);
    let t = g.coords_tensor();
    assert_eq!(t.size(), vec![3, 3]);
    assert_eq!(t.int64_value(&[2, 0]), 2);
}

fn brute_force_check(g: &SparseGrid, k: usize) {
    let index: HashMap<u64, usize> = g.keys().iter().enumerate().map(|(i, &k)| (k, i)).collect();
    let map = g.kernel_map(k).unwrap();
    assert_eq!(map.rows(), g.len());
    assert_eq!(map.tensor(Device::Cpu).size(), vec![g.len() as i64, (k * k * k) as i64]);
    for i in 0..g.len() {
        let (b, c) = unpack_key(g.keys()[i]);
        for o in 0..k * k * k {
            let d = KernelMap::offset_of(k, o);
            assert_eq!(KernelMap::column_of(k, d), o);
            let want = index.get(&pack_key(b, c + d)).map(|&j| j as i64).unwrap_or(g.len() as i64);
            assert_eq!(map.neighbours(i)[o], want, "voxel {c} batch {b} offset {d} k {k}");
        }
    }
}

#[test]
fn kernel_maps_match_brute_force() {
    let mut rng = Rng::new(7);
    // Dense-ish and sparse sets, negative coordinates, more rows than one block.
    for (n, lo, size) in [(300, -4, 8), (6000, -10, 20), (5000, 0, 60)] {
        let g = SparseGrid::from_coords(32, &random_coords(&mut rng, n, lo, size)).unwrap();
        for k in [1, 3, 5] {
            brute_force_check(&g, k);
        }
    }
    // Batched: neighbours never cross items even where coordinates coincide.
    let a = SparseGrid::from_coords(16, &random_coords(&mut rng, 400, 0, 8)).unwrap();
    let b = SparseGrid::from_coords(16, &random_coords(&mut rng, 400, 0, 8)).unwrap();
    let ab = SparseGrid::batch(&[&a, &b]).unwrap();
    for k in [3, 5] {
        brute_force_check(&ab, k);
    }
    // Cached: the same Arc comes back.
    assert!(Arc::ptr_eq(&ab.kernel_map(3).unwrap(), &ab.kernel_map(3).unwrap()));
    assert!(ab.kernel_map(4).is_err());
    // Empty grid.
    assert_eq!(SparseGrid::empty(4).kernel_map(3).unwrap().as_slice().len(), 0);
}

#[test]
fn subdivision_children_and_parents() {
    let coords = [IVec3::new(0, 0, 0), IVec3::new(0, 1, 0), IVec3::new(3, -1, 2), IVec3::new(0, 0, 1)];
    let g = SparseGrid::from_coords(4, &coords).unwrap();
    let s = g.subdivide().unwrap();
    assert_eq!(s.fine.resolution(), 8);
    assert_eq!(s.fine.len(), 32);
    let mut want: Vec<u64> = Vec::new();
    for &c in &coords {
        for code in 0..8 {
            want.push(pack_key(0, c * 2 + IVec3::new(code >> 2, (code >> 1) & 1, code & 1)));
        }
    }
    want.sort();
    assert_eq!(s.fine.keys(), &want[..]);
    for i in 0..s.fine.len() {
        let p = g.coord(s.parent[i] as usize);
        let code = s.child[i] as i32;
        assert_eq!(s.fine.coord(i), p * 2 + IVec3::new(code >> 2, (code >> 1) & 1, code & 1));
    }
    assert!(Arc::ptr_eq(&g.subdivide().unwrap().fine, &s.fine));
    // Batched subdivision keeps items apart and sorted.
    let gb = SparseGrid::batch(&[&g, &g]).unwrap();
    let sb = gb.subdivide().unwrap();
    assert_eq!(sb.fine.len(), 64);
    assert_eq!(sb.fine.batch_size(), Some(2));
    assert!(sb.fine.keys().windows(2).all(|w| w[0] < w[1]));
    assert_eq!(sb.parent[40], s.parent[8] + 4);
}

#[test]
fn prune_crop_dilate_dense_box() {
    let coords = [IVec3::new(1, 1, 1), IVec3::new(2, 5, 1), IVec3::new(4, 2, 3), IVec3::new(9, 9, 9)];
    let g = SparseGrid::from_coords(16, &coords).unwrap();
    let (p, rows) = g.prune(&[true, false, true, false]).unwrap();
    assert_eq!(p.coords(), vec![IVec3::new(1, 1, 1), IVec3::new(4, 2, 3)]);
    assert_eq!(rows, vec![0, 2]);
    assert!(g.prune(&[true]).is_err());

    let (c, rows) = g.crop(IVec3::new(2, 2, 2), 0, 5); // [0, 5)
    assert_eq!(c.coords(), vec![IVec3::new(1, 1, 1), IVec3::new(4, 2, 3)]);
    assert_eq!(rows, vec![0, 2]);
    let (c, _) = g.crop(IVec3::new(2, 2, 2), 0, 4); // [0, 4)
    assert_eq!(c.coords(), vec![IVec3::new(1, 1, 1)]);

    let single = SparseGrid::from_coords(16, &[IVec3::new(0, 0, 0)]).unwrap();
    let d = single.dilate(1).unwrap();
    assert_eq!(d.len(), 27);
    assert_eq!(d.coords()[0], IVec3::splat(-1));
    let two = SparseGrid::from_coords(16, &[IVec3::ZERO, IVec3::new(2, 0, 0)]).unwrap();
    assert_eq!(two.dilate(1).unwrap().len(), 2 * 27 - 9);
    assert_eq!(two.dilate(2).unwrap().len(), 7 * 25);
    // dilation equals the union of neighbourhoods (brute force)
    let mut rng = Rng::new(3);
    let r = SparseGrid::from_coords(16, &random_coords(&mut rng, 50, 0, 10)).unwrap();
    let mut want = HashSet::new();
    for c in r.coords() {
        for o in 0..125 {
            want.insert(c + KernelMap::offset_of(5, o));
        }
    }
    let mut want: Vec<IVec3> = want.into_iter().collect();
    want.sort_by_key(|c| (c.x, c.y, c.z));
    assert_eq!(r.dilate(2).unwrap().coords(), want);

    let (bx, index) = g.dense_box().unwrap();
    assert_eq!(bx.len(), 9 * 9 * 9);
    assert_eq!(bx.coords()[0], IVec3::splat(1));
    for (i, &j) in index.iter().enumerate() {
        assert_eq!(bx.coord(j as usize), g.coord(i));
    }
    assert_eq!(g.lookup(&bx).iter().filter(|&&j| j >= 0).count(), 4);
}

#[test]
fn batching_and_splitting() {
    let a = SparseGrid::from_coords(8, &[IVec3::new(5, 5, 5), IVec3::new(0, 0, 0)]).unwrap();
    let b = SparseGrid::from_coords(8, &[IVec3::new(1, 2, 3)]).unwrap();
    let ab = SparseGrid::batch(&[&a, &b]).unwrap();
    assert_eq!(ab.len(), 3);
    assert_eq!(ab.batch_indices(), vec![0, 0, 1]);
    assert_eq!(ab.batch_ranges(), vec![0..2, 2..3]);
    assert_eq!(ab.find(IVec3::new(1, 2, 3), 1), Some(2));
    assert_eq!(ab.find(IVec3::new(1, 2, 3), 0), None);
    let parts = ab.split();
    assert_eq!(parts[0].0, a);
    assert_eq!(parts[1].0, b);
    assert_eq!(parts[1].1, 2..3);
    assert!(SparseGrid::batch(&[&ab, &a]).is_err());
    let c = SparseGrid::from_coords(16, &[IVec3::ZERO]).unwrap();
    assert!(SparseGrid::batch(&[&a, &c]).is_err());
    // dense box per item
    let (bx, index) = ab.dense_box().unwrap();
    assert_eq!(bx.len(), 6 * 6 * 6 + 1);
    assert_eq!(index, vec![0, 215, 216]);
    // crop picks one item and drops the batch index
    let (cb, rows) = ab.crop(IVec3::new(1, 2, 3), 1, 3);
    assert_eq!((cb.coords(), rows, cb.batch_size()), (vec![IVec3::new(1, 2, 3)], vec![2], None));
    let from_batched =
        SparseGrid::from_batched_coords(8, &[IVec3::new(1, 2, 3), IVec3::new(0, 0, 0), IVec3::new(5, 5, 5)], &[1, 0, 0], 2)
            .unwrap();
    assert_eq!(from_batched, ab);
}

/// A batch's halves are batches of its whole items, the first half rounded
/// up, the second's items numbered from 0; cached; none for one item.
#[test]
fn halves_cut_a_batch_between_whole_items() {
    let a = SparseGrid::from_coords(8, &[IVec3::new(5, 5, 5), IVec3::new(0, 0, 0)]).unwrap();
    let b = SparseGrid::from_coords(8, &[IVec3::new(1, 2, 3)]).unwrap();
    let c = SparseGrid::from_coords(8, &[IVec3::new(7, 7, 7), IVec3::new(2, 2, 2), IVec3::new(3, 3, 3)]).unwrap();
    let abc = SparseGrid::batch(&[&a, &b, &c]).unwrap();
    let h = abc.halves().expect("three items have halves");
    assert_eq!(h.split_row, 3);
    assert_eq!(*h.first, SparseGrid::batch(&[&a, &b]).unwrap());
    assert_eq!(*h.second, SparseGrid::batch(&[&c]).unwrap());
    assert!(Arc::ptr_eq(&h, &abc.halves().unwrap()), "computed once");
    assert!(a.halves().is_none() && SparseGrid::batch(&[&a]).unwrap().halves().is_none());
}
