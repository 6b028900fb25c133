//! The subdivision of a coarse grid into its 2x2x2 children (the upsampler's and the
//! finer level's grid).

use super::*;

/// A coarse grid subdivided into the 8 children of each voxel.
pub struct Subdivision {
    /// The fine grid (resolution doubled), sorted like every grid.
    pub fine: Arc<SparseGrid>,
    /// For each fine voxel, the row of its parent in the coarse grid.
    pub parent: Vec<i64>,
    /// For each fine voxel, its child code `a * 4 + b * 2 + c` where the child's
    /// coordinate is `2 * parent + (a, b, c)`.
    pub child: Vec<u8>,
    pub(super) source: DeviceCache,
}

impl std::fmt::Debug for Subdivision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Subdivision {{ fine: {} voxels }}", self.fine.len())
    }
}

impl Subdivision {
    /// `parent * 8 + child` per fine voxel as an int64 tensor on `device`: the row of
    /// a `[N_coarse * 8, C]` view of per-parent, per-child values.
    pub fn source_tensor(&self, device: Device) -> Tensor {
        self.source.get(device, || {
            let v: Vec<i64> = self
                .parent
                .par_iter()
                .zip(self.child.par_iter())
                .map(|(&p, &c)| p * 8 + c as i64)
                .collect();
            Tensor::from_slice(&v)
        })
    }
}
