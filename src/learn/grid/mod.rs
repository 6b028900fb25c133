//! @brief The sparse voxel grid: a sorted set of unique voxel coordinates and the
//! bulk topology operations the networks need (kernel maps, subdivision, pruning,
//! dense boxes, crops, dilation, batching).
//!
//! # Representation
//!
//! A voxel is packed into one `u64` key, `batch << 48 | (x + B) << 32 | (y + B) << 16 |
//! (z + B)` with the bias `B = 2^15`, so that sorting keys sorts voxels by
//! (batch, x, y, z) and a neighbour at offset `(dx, dy, dz)` has the key
//! `key + dx * 2^32 + dy * 2^16 + dz`. Coordinates are in voxel units of the grid's
//! resolution and must lie in `[-COORD_LIMIT, COORD_LIMIT)`; the remaining headroom of
//! each 16-bit field makes neighbour arithmetic exact (it never carries into the next
//! field), so neighbours can never cross a batch item or wrap around an axis.
//!
//! A grid is immutable; every operation returns a new grid. Kernel maps and the
//! subdivision are computed on first use and cached inside the grid (`OnceLock`),
//! so sharing the grid through an `Arc` shares them too.
//!
//! # Kernel maps
//!
//! [`SparseGrid::kernel_map`]`(k)` is an `[N, k^3]` row-major `i64` table: entry
//! `(i, o)` is the row of the neighbour of voxel `i` at offset `o`, or `N` (one past
//! the last row) when that neighbour is not active. The offset index is
//! `o = ((dx + r) * k + (dy + r)) * k + (dz + r)`, `r = k / 2`: the same order as the
//! `(kd, kh, kw)` axes of a dense `conv3d` weight over a tensor indexed `[x][y][z]`.
//! The convolution appends one zero row to its features so that `N` reads zeros.
//!
//! It is built in three steps, in parallel over blocks of rows, each row's `k^3`
//! entries written once, in order:
//! 1. per block, one cursor per (dx, dy) column, placed by binary search at the
//!    block's first key shifted by `dx * 2^32 + dy * 2^16 - r`;
//! 2. per row and column, the cursor moves forward to the first key >= the row's
//!    shifted key (rows and keys are both sorted: a merge, no hashing);
//! 3. the z-neighbours `dz = -r..=r` are then consecutive keys: each slot gets the
//!    matching row or the missing value `N`.
//!
//! On a ~1.8M-voxel grid the k = 5 table is 1.8 GB; first-touching that fresh
//! memory, not the merge, is most of its build time.
//!
//! No operation allocates a dense array of the full cube; [`SparseGrid::dense_box`]
//! allocates the bounding box of the active voxels, which is what it is for.

use std::ops::Range;
use std::sync::{Arc, Mutex, OnceLock};

use glam::IVec3;
use rayon::prelude::*;
use tch::{Device, Kind, Tensor};

/// Coordinates (voxel units) must lie in `[-COORD_LIMIT, COORD_LIMIT)` on every axis.
pub const COORD_LIMIT: i32 = 1 << 14;
/// At most this many items in a batched grid.
pub const MAX_BATCH: usize = 1 << 16;
/// Kernel sizes whose maps are cached: 1, 3, 5, 7.
pub const MAX_KERNEL_SIZE: usize = 7;

const BIAS: i32 = 1 << 15;
const FIELD_MASK: u64 = 0xFFFF;
/// Rows per parallel block when building kernel maps.
const KMAP_BLOCK_ROWS: usize = 2048;

/// Errors of grid construction and topology operations.
#[derive(Debug, thiserror::Error)]
pub enum GridError {
    #[error("voxel {0} is outside the supported coordinate range [-{l}, {l})", l = COORD_LIMIT)]
    OutOfRange(IVec3),
    #[error("voxel {0} appears more than once")]
    Duplicate(IVec3),
    #[error("kernel size {0} is not supported (odd, 1..={max})", max = MAX_KERNEL_SIZE)]
    KernelSize(usize),
    #[error("{0}")]
    Invalid(String),
}

crate::stage_error!(GridError);

type GridResult<T> = std::result::Result<T, GridError>;

mod kernel_map;
mod key;
mod subdivision;
pub use kernel_map::KernelMap;
pub use key::{pack_key, unpack_key};
use kernel_map::*;
use key::*;
pub use subdivision::Subdivision;

/// Sorted unique voxels of one grid, or of a batch of grids of equal resolution.
#[derive(Clone)]
pub struct SparseGrid {
    resolution: u32,
    keys: Vec<u64>,
    batch_size: Option<usize>,
    kernel_maps: [OnceLock<Arc<KernelMap>>; MAX_KERNEL_SIZE.div_ceil(2)],
    subdivision: OnceLock<Arc<Subdivision>>,
    halves: OnceLock<Option<Arc<Halves>>>,
}

/// A batch cut into two batches of whole items ([`SparseGrid::halves`]): the
/// first holds the first half of the items (rounded up), the rows before
/// `split_row`; the second the rest, its items numbered from 0.
#[derive(Debug)]
pub struct Halves {
    pub first: Arc<SparseGrid>,
    pub second: Arc<SparseGrid>,
    pub split_row: usize,
}

impl std::fmt::Debug for SparseGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "SparseGrid {{ resolution: {}, voxels: {}, batch_size: {:?} }}",
            self.resolution,
            self.keys.len(),
            self.batch_size
        )
    }
}

impl PartialEq for SparseGrid {
    fn eq(&self, other: &Self) -> bool {
        self.resolution == other.resolution
            && self.batch_size == other.batch_size
            && self.keys == other.keys
    }
}

impl SparseGrid {
    fn from_sorted_keys(resolution: u32, keys: Vec<u64>, batch_size: Option<usize>) -> Self {
        debug_assert!(keys.windows(2).all(|w| w[0] < w[1]));
        SparseGrid {
            resolution,
            keys,
            batch_size,
            kernel_maps: Default::default(),
            subdivision: OnceLock::new(),
            halves: OnceLock::new(),
        }
    }

    fn check_coords(coords: &[IVec3]) -> GridResult<()> {
        match coords.par_iter().find_any(|c| !in_range(**c)) {
            Some(c) => Err(GridError::OutOfRange(*c)),
            None => Ok(()),
        }
    }

    /// The empty grid.
    pub fn empty(resolution: u32) -> Self {
        Self::from_sorted_keys(resolution, Vec::new(), None)
    }

    /// A grid of the given voxels, in any order; duplicates are merged.
    pub fn from_coords(resolution: u32, coords: &[IVec3]) -> GridResult<Self> {
        Self::check_coords(coords)?;
        let mut keys: Vec<u64> = coords.par_iter().map(|&c| pack_key(0, c)).collect();
        keys.par_sort_unstable();
        keys.dedup();
        Ok(Self::from_sorted_keys(resolution, keys, None))
    }

    /// A grid of the given voxels, in any order, which must be unique. Also returns
    /// `order`: grid row `i` is `coords[order[i]]` (to permute per-voxel data).
    pub fn from_unique_coords(resolution: u32, coords: &[IVec3]) -> GridResult<(Self, Vec<usize>)> {
        Self::check_coords(coords)?;
        let mut pairs: Vec<(u64, usize)> =
            coords.par_iter().enumerate().map(|(i, &c)| (pack_key(0, c), i)).collect();
        pairs.par_sort_unstable();
        if let Some(w) = pairs.par_windows(2).find_any(|w| w[0].0 == w[1].0) {
            return Err(GridError::Duplicate(unpack_key(w[0].0).1));
        }
        let (keys, order): (Vec<u64>, Vec<usize>) = pairs.into_par_iter().unzip();
        Ok((Self::from_sorted_keys(resolution, keys, None), order))
    }

    /// A batched grid from voxels with a batch index each (`batch_size` items);
    /// duplicates within an item are merged.
    pub fn from_batched_coords(
        resolution: u32,
        coords: &[IVec3],
        batch: &[u32],
        batch_size: usize,
    ) -> GridResult<Self> {
        if coords.len() != batch.len() {
            return Err(GridError::Invalid(format!(
                "{} coordinates but {} batch indices",
                coords.len(),
                batch.len()
            )));
        }
        if batch_size > MAX_BATCH || batch.par_iter().any(|&b| b as usize >= batch_size) {
            return Err(GridError::Invalid(format!(
                "batch indices must be below the batch size {batch_size} (at most {MAX_BATCH})"
            )));
        }
        Self::check_coords(coords)?;
        let mut keys: Vec<u64> =
            coords.par_iter().zip(batch.par_iter()).map(|(&c, &b)| pack_key(b, c)).collect();
        keys.par_sort_unstable();
        keys.dedup();
        Ok(Self::from_sorted_keys(resolution, keys, Some(batch_size)))
    }

    /// Every voxel of the box `[min, min + size)` (an unbatched dense grid).
    pub fn full_box(resolution: u32, min: IVec3, size: IVec3) -> GridResult<Self> {
        let keys = Self::box_keys(0, min, size)?;
        Ok(Self::from_sorted_keys(resolution, keys, None))
    }

    fn box_keys(batch: u32, min: IVec3, size: IVec3) -> GridResult<Vec<u64>> {
        if size.cmple(IVec3::ZERO).any() {
            return Ok(Vec::new());
        }
        for c in [min, min + size - IVec3::ONE] {
            if !in_range(c) {
                return Err(GridError::OutOfRange(c));
            }
        }
        let (sy, sz) = (size.y as usize, size.z as usize);
        let n = size.x as usize * sy * sz;
        Ok((0..n)
            .into_par_iter()
            .map(|i| {
                let c = IVec3::new((i / (sy * sz)) as i32, ((i / sz) % sy) as i32, (i % sz) as i32);
                pack_key(batch, min + c)
            })
            .collect())
    }

    // ----------------------------------------------------------------- accessors

    /// Voxels per axis over the normalised cube [-1, 1].
    pub fn resolution(&self) -> u32 {
        self.resolution
    }
    pub fn len(&self) -> usize {
        self.keys.len()
    }
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }
    /// `Some(items)` for a batched grid, `None` for a single grid.
    pub fn batch_size(&self) -> Option<usize> {
        self.batch_size
    }
    /// The sorted packed keys (see the module documentation).
    pub fn keys(&self) -> &[u64] {
        &self.keys
    }
    pub fn coord(&self, i: usize) -> IVec3 {
        unpack_key(self.keys[i]).1
    }
    pub fn coords(&self) -> Vec<IVec3> {
        self.keys.par_iter().map(|&k| unpack_key(k).1).collect()
    }
    pub fn batch_indices(&self) -> Vec<u32> {
        self.keys.par_iter().map(|&k| unpack_key(k).0).collect()
    }
    /// Coordinates as an `[N, 3]` int64 CPU tensor.
    pub fn coords_tensor(&self) -> Tensor {
        let flat: Vec<i64> = self
            .keys
            .par_iter()
            .flat_map_iter(|&k| {
                let c = unpack_key(k).1;
                [c.x as i64, c.y as i64, c.z as i64]
            })
            .collect();
        Tensor::from_slice(&flat).view([self.len() as i64, 3])
    }
    /// Row range of each batch item (one range for an unbatched grid).
    pub fn batch_ranges(&self) -> Vec<Range<usize>> {
        let items = self.batch_size.unwrap_or(1);
        let starts: Vec<usize> = (0..=items)
            .map(|b| self.keys.partition_point(|&k| (k >> 48) < b as u64))
            .collect();
        starts.windows(2).map(|w| w[0]..w[1]).collect()
    }
    /// Row of voxel `c` of batch item `batch`, if active.
    pub fn find(&self, c: IVec3, batch: u32) -> Option<usize> {
        if !in_range(c) {
            return None;
        }
        self.keys.binary_search(&pack_key(batch, c)).ok()
    }
    /// For every voxel of `other` (same batch layout), its row in `self` or -1.
    /// A merge of the two sorted key arrays, in parallel blocks.
    pub fn lookup(&self, other: &SparseGrid) -> Vec<i64> {
        let mut out = vec![-1i64; other.len()];
        out.par_chunks_mut(8192).enumerate().for_each(|(ci, block)| {
            let q = &other.keys[ci * 8192..ci * 8192 + block.len()];
            let mut p = self.keys.partition_point(|&k| k < q[0]);
            for (o, &key) in block.iter_mut().zip(q) {
                while p < self.keys.len() && self.keys[p] < key {
                    p += 1;
                }
                if p < self.keys.len() && self.keys[p] == key {
                    *o = p as i64;
                }
            }
        });
        out
    }
    /// Inclusive bounding box `(min, max)` of each batch item (`None` if empty).
    pub fn bounding_boxes(&self) -> Vec<Option<(IVec3, IVec3)>> {
        self.batch_ranges()
            .into_iter()
            .map(|r| {
                self.keys[r]
                    .par_iter()
                    .map(|&k| {
                        let c = unpack_key(k).1;
                        (c, c)
                    })
                    .reduce_with(|a, b| (a.0.min(b.0), a.1.max(b.1)))
            })
            .collect()
    }

    // ----------------------------------------------------------------- kernel maps

    /// The cached `[N, k^3]` neighbour table for odd `k` in 1..=7 (see the module
    /// documentation): computed on first use, shared afterwards.
    pub fn kernel_map(&self, k: usize) -> GridResult<Arc<KernelMap>> {
        if k.is_multiple_of(2) || k > MAX_KERNEL_SIZE {
            return Err(GridError::KernelSize(k));
        }
        Ok(self.kernel_maps[k / 2].get_or_init(|| Arc::new(self.build_kernel_map(k))).clone())
    }

    fn build_kernel_map(&self, k: usize) -> KernelMap {
        let n = self.len();
        let k3 = k * k * k;
        let r = (k / 2) as i64;
        let cpu = Tensor::empty([n as i64, k3 as i64], (Kind::Int64, Device::Cpu));
        if n > 0 {
            // SAFETY: freshly allocated contiguous int64 tensor of n * k3 elements,
            // written only here, before anyone else can see it.
            let table = unsafe { std::slice::from_raw_parts_mut(cpu.data_ptr() as *mut i64, n * k3) };
            // The keys followed by k + 1 copies of u64::MAX: every cursor stops inside
            // the array without a bounds test, and the slot loop below runs branch-free.
            let mut padded = Vec::with_capacity(n + k + 1);
            padded.extend_from_slice(&self.keys);
            padded.resize(n + k + 1, u64::MAX);
            let keys = &padded[..];
            // One key offset per (dx, dy) column, in column order.
            let deltas: Vec<u64> = (-r..=r)
                .flat_map(|dx| (-r..=r).map(move |dy| key_delta(IVec3::new(dx as i32, dy as i32, 0))))
                .collect();
            let missing = n as i64;
            table.par_chunks_mut(KMAP_BLOCK_ROWS * k3).enumerate().for_each(|(ci, block)| {
                let i0 = ci * KMAP_BLOCK_ROWS;
                let block_keys = &keys[i0..i0 + block.len() / k3];
                // Step 1: a cursor per (dx, dy) column at the block's first row.
                let mut cursors: Vec<usize> = deltas
                    .iter()
                    .map(|&d| {
                        let lo = block_keys[0].wrapping_add(d).wrapping_sub(r as u64);
                        keys[..n].partition_point(|&key| key < lo)
                    })
                    .collect();
                for (&key, row) in block_keys.iter().zip(block.chunks_exact_mut(k3)) {
                    for ((&d, p), out) in deltas.iter().zip(cursors.iter_mut()).zip(row.chunks_exact_mut(k)) {
                        // Step 2: advance this column's cursor to the first key >= lo.
                        let lo = key.wrapping_add(d).wrapping_sub(r as u64);
                        while keys[*p] < lo {
                            *p += 1;
                        }
                        // Step 3: the z-neighbours lo..=lo+2r are consecutive keys.
                        let mut q = *p;
                        for (dz, slot) in out.iter_mut().enumerate() {
                            let hit = keys[q] == lo.wrapping_add(dz as u64);
                            *slot = if hit { q as i64 } else { missing };
                            q += hit as usize;
                        }
                    }
                }
            });
        }
        KernelMap { kernel_size: k, rows: n, cpu: FrozenTensor(cpu), devices: DeviceCache::new() }
    }

    // ----------------------------------------------------------------- topology

    /// The 8 children of every voxel (resolution doubled), with child->parent rows.
    /// Cached: every caller gets the same `Arc` fine grid.
    pub fn subdivide(&self) -> GridResult<Arc<Subdivision>> {
        if let Some(s) = self.subdivision.get() {
            return Ok(s.clone());
        }
        if let Some(&k) = self.keys.par_iter().find_any(|&&k| {
            let c = unpack_key(k).1 * 2;
            !in_range(c) || !in_range(c + IVec3::ONE)
        }) {
            return Err(GridError::OutOfRange(unpack_key(k).1 * 2));
        }
        Ok(self.subdivision.get_or_init(|| Arc::new(self.build_subdivision())).clone())
    }

    fn build_subdivision(&self) -> Subdivision {
        // Children come out sorted without a sort: within a slab of parents with equal
        // (batch, x), children are ordered by a, then parent row y, then b, then parent
        // z, then c.
        let keys = &self.keys;
        let slab_starts: Vec<usize> = (0..keys.len())
            .into_par_iter()
            .filter(|&i| i == 0 || keys[i] >> 32 != keys[i - 1] >> 32)
            .chain(rayon::iter::once(keys.len()))
            .collect();
        let (fine_keys, source): (Vec<u64>, Vec<u64>) = slab_starts
            .par_windows(2)
            .flat_map_iter(|w| {
                let (s, e) = (w[0], w[1]);
                // rows within the slab
                let mut rows = vec![s];
                for i in s + 1..e {
                    if keys[i] >> 16 != keys[i - 1] >> 16 {
                        rows.push(i);
                    }
                }
                rows.push(e);
                let mut out = Vec::with_capacity((e - s) * 8);
                for a in 0..2 {
                    for rw in rows.windows(2) {
                        for b in 0..2 {
                            for (i, &key) in keys.iter().enumerate().take(rw[1]).skip(rw[0]) {
                                let (batch, p) = unpack_key(key);
                                for c in 0..2 {
                                    let child = p * 2 + IVec3::new(a, b, c);
                                    let code = (a * 4 + b * 2 + c) as u64;
                                    out.push((pack_key(batch, child), (i as u64) << 3 | code));
                                }
                            }
                        }
                    }
                }
                out
            })
            .unzip();
        let parent: Vec<i64> = source.par_iter().map(|&s| (s >> 3) as i64).collect();
        let child: Vec<u8> = source.par_iter().map(|&s| (s & 7) as u8).collect();
        let fine = Arc::new(Self::from_sorted_keys(self.resolution * 2, fine_keys, self.batch_size));
        Subdivision { fine, parent, child, source: DeviceCache::new() }
    }

    /// The voxels with `keep[i]`, and the rows they came from.
    pub fn prune(&self, keep: &[bool]) -> GridResult<(SparseGrid, Vec<i64>)> {
        if keep.len() != self.len() {
            return Err(GridError::Invalid(format!(
                "prune mask has {} entries for {} voxels",
                keep.len(),
                self.len()
            )));
        }
        let rows: Vec<i64> =
            (0..self.len()).into_par_iter().filter(|&i| keep[i]).map(|i| i as i64).collect();
        let keys = rows.par_iter().map(|&i| self.keys[i as usize]).collect();
        Ok((Self::from_sorted_keys(self.resolution, keys, self.batch_size), rows))
    }

    /// Every voxel of each batch item's bounding box, and for every voxel of `self`
    /// its row in the box grid.
    pub fn dense_box(&self) -> GridResult<(SparseGrid, Vec<i64>)> {
        let boxes = self.bounding_boxes();
        let ranges = self.batch_ranges();
        let mut keys = Vec::new();
        let mut index = vec![0i64; self.len()];
        for (b, (bx, range)) in boxes.iter().zip(ranges).enumerate() {
            let Some((lo, hi)) = *bx else { continue };
            let size = hi - lo + IVec3::ONE;
            let base = keys.len() as i64;
            keys.extend(Self::box_keys(b as u32, lo, size)?);
            let (sy, sz) = (size.y as i64, size.z as i64);
            index[range.clone()].par_iter_mut().zip(&self.keys[range]).for_each(|(o, &k)| {
                let c = unpack_key(k).1 - lo;
                *o = base + (c.x as i64 * sy + c.y as i64) * sz + c.z as i64;
            });
        }
        Ok((Self::from_sorted_keys(self.resolution, keys, self.batch_size), index))
    }

    /// The voxels of batch item `batch` inside the box of `size` voxels per axis
    /// around `centre` (`[centre - size/2, centre - size/2 + size)`, so 41 gives
    /// centre +- 20), as an unbatched grid, and the rows they came from.
    pub fn crop(&self, centre: IVec3, batch: u32, size: i32) -> (SparseGrid, Vec<i64>) {
        let lo = centre - IVec3::splat(size / 2);
        let hi = lo + IVec3::splat(size); // exclusive
        let clamp = |c: IVec3| c.clamp(IVec3::splat(-COORD_LIMIT), IVec3::splat(COORD_LIMIT));
        let (lo, hi) = (clamp(lo), clamp(hi));
        if size <= 0 || lo.cmpge(hi).any() {
            return (Self::empty(self.resolution), Vec::new());
        }
        // Keys are sorted by (batch, x): the x range is one contiguous run.
        let first = pack_key(batch, IVec3::new(lo.x, -COORD_LIMIT, -COORD_LIMIT));
        let last = pack_key(batch, IVec3::new(hi.x, -COORD_LIMIT, -COORD_LIMIT));
        let s = self.keys.partition_point(|&k| k < first);
        let e = self.keys.partition_point(|&k| k < last);
        let rows: Vec<i64> = (s..e)
            .into_par_iter()
            .filter(|&i| {
                let c = unpack_key(self.keys[i]).1;
                c.y >= lo.y && c.y < hi.y && c.z >= lo.z && c.z < hi.z
            })
            .map(|i| i as i64)
            .collect();
        let keys = rows.par_iter().map(|&i| strip_batch(self.keys[i as usize])).collect();
        (Self::from_sorted_keys(self.resolution, keys, None), rows)
    }

    /// All voxels within Chebyshev distance `radius` of an active voxel (a cube
    /// dilation, done as three separable 1-D passes), same batch layout.
    pub fn dilate(&self, radius: i32) -> GridResult<SparseGrid> {
        if radius < 0 {
            return Err(GridError::Invalid(format!("negative dilation radius {radius}")));
        }
        for bb in self.bounding_boxes().into_iter().flatten() {
            for c in [bb.0 - IVec3::splat(radius), bb.1 + IVec3::splat(radius)] {
                if !in_range(c) {
                    return Err(GridError::OutOfRange(c));
                }
            }
        }
        let mut keys = self.keys.clone();
        for axis in [IVec3::Z, IVec3::Y, IVec3::X] {
            let mut next: Vec<u64> = keys
                .par_iter()
                .flat_map_iter(|&k| (-radius..=radius).map(move |d| k.wrapping_add(key_delta(axis * d))))
                .collect();
            next.par_sort_unstable();
            next.dedup();
            keys = next;
        }
        Ok(Self::from_sorted_keys(self.resolution, keys, self.batch_size))
    }

    /// Concatenates unbatched grids of equal resolution into one batched grid; grid
    /// `b` becomes batch item `b` and its rows follow those of grid `b - 1`.
    pub fn batch(grids: &[&SparseGrid]) -> GridResult<SparseGrid> {
        let Some(first) = grids.first() else {
            return Err(GridError::Invalid("cannot batch zero grids".into()));
        };
        if grids.len() > MAX_BATCH {
            return Err(GridError::Invalid(format!("at most {MAX_BATCH} grids in a batch")));
        }
        for g in grids {
            if g.resolution != first.resolution {
                return Err(GridError::Invalid(format!(
                    "cannot batch grids of resolutions {} and {}",
                    first.resolution, g.resolution
                )));
            }
            if g.batch_size.is_some() {
                return Err(GridError::Invalid("cannot batch a grid that is already batched".into()));
            }
        }
        let mut keys = Vec::with_capacity(grids.iter().map(|g| g.len()).sum());
        for (b, g) in grids.iter().enumerate() {
            keys.par_extend(g.keys.par_iter().map(|&k| ((b as u64) << 48) | k));
        }
        Ok(Self::from_sorted_keys(first.resolution, keys, Some(grids.len())))
    }

    /// The batch cut into two batches of whole items (None for fewer than two
    /// items), computed on first use and cached like the kernel maps, so a
    /// batch used again (level 0's training batch, every step) cuts once
    /// and each half keeps its own cached kernel maps.
    pub fn halves(&self) -> Option<Arc<Halves>> {
        self.halves
            .get_or_init(|| {
                let items = self.batch_size.filter(|&b| b >= 2)?;
                let first_items = items.div_ceil(2);
                let split_row = self.batch_ranges()[first_items].start;
                let rebase = (first_items as u64) << 48;
                let first = Self::from_sorted_keys(self.resolution, self.keys[..split_row].to_vec(), Some(first_items));
                let second_keys = self.keys[split_row..].iter().map(|&k| k - rebase).collect();
                let second = Self::from_sorted_keys(self.resolution, second_keys, Some(items - first_items));
                Some(Arc::new(Halves { first: Arc::new(first), second: Arc::new(second), split_row }))
            })
            .clone()
    }

    /// The items of a batched grid as unbatched grids with their row ranges (an
    /// unbatched grid gives itself and `0..len`).
    pub fn split(&self) -> Vec<(SparseGrid, Range<usize>)> {
        self.batch_ranges()
            .into_iter()
            .map(|r| {
                let keys = self.keys[r.clone()].par_iter().map(|&k| strip_batch(k)).collect();
                (Self::from_sorted_keys(self.resolution, keys, None), r)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests;
